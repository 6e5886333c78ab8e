"""pyomo_heli: multi-objective parameter identification of nonlinear helicopter flight models."""
__version__ = "0.1.0"
