"""OpenSim tool setups (``<OpenSimDocument><...Tool>``) run by pinmsk."""
