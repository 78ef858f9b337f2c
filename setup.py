"""Packaging: the kernels of the checkout's top-level ``generated/`` ship in the wheel as ``pige_sym.generated``.

Everything else is in ``pyproject.toml``; this file only adds that one folder mapping, which the
``[tool.setuptools.packages.find]`` table cannot express.
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["pige_sym*"]), "pige_sym.generated"],
    package_dir={"pige_sym.generated": "generated"},
    package_data={"pige_sym.generated": ["*.py"]},
)
