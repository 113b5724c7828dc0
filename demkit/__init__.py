"""demkit: Python side of the DEM toolkit (reading curves, plots, comparisons).

Runs on Debian's /usr/bin/python3 with python3-numpy and python3-matplotlib.
"""
