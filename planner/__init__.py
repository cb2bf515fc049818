"""Shore-side planner: forecast -> grid -> transitions -> solve -> policy table.

Importing this package does no work and pulls in nothing heavy: the executive
imports ``planner.contract.table`` and must not load xarray, scipy or numba.
"""

__version__ = "0.1.0"
