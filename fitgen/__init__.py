"""fitgen: sensor physics, stepwise AIC fitting and C generation for a magnetic tactile sensor."""

__version__ = "0.1.0"
