"""fbmflow: particulate flows with the finite element fictitious boundary method."""
__version__ = "0.1.0"
