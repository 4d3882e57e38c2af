"""Runners of OpenSim tool setup files."""
