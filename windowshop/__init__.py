"""windowshop: photos of an object -> Neural Radiance Field -> 360° turntable video."""

__version__ = "0.1.0"
