"""OpenSim model layer: skeletons, functions, muscle paths and muscles built from an .osim document."""
