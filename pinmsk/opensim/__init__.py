"""OpenSim models in pinmsk: the model layer of the .osim import (skeleton, functions, paths, muscles)."""
