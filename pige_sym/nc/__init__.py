"""NC programs: a modal G-code interpreter and guarded rewriting for compensation.

``lexer`` (tokens with offsets) → ``dialects`` (what each code means: 840D, ISO/Fanuc/Haas,
LinuxCNC) and ``detect`` → ``state`` + ``interpreter`` (modal state and pose through every
block) → ``compensate`` (plan, guards, report) → ``rewrite`` (only the digits needed) →
``verify`` (read-back).  ``program`` reads programs for the rest of the tool and writes R-test
programs; ``rtest_program`` turns them into measurement schedules.
"""
