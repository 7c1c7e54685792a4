"""Solver machinery shared by the FEM, contact and rod simulators."""
