"""mirrorsim: a physically rendered simulator of a mirror space for NLOS localization."""

__version__ = "0.2.0"
