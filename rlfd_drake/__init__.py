"""rlfd_drake: residual Learning from Demonstration (Davchev et al., RA-L 2022) on Drake."""

__version__ = "0.1.0"
