"""Datasets to and from other tools: export (HDF5, LeRobot) and import (recordings)."""
