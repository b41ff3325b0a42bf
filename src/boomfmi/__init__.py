"""boomfmi: a pneumatic excavator boom as FMI 2.0 co-simulation components."""
__version__ = "0.1.0"

__all__ = ["__version__"]
