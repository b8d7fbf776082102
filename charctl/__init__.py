"""charctl: training and evaluation toolkit for physics-based and data-driven character animation."""

__version__ = "0.1.0"
