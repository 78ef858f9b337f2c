"""Compensated kinematics (model side) and controller corrections; :mod:`pige_sym.nc` is the G-code side."""
