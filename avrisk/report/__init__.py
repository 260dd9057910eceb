"""Plots, animations and the HTML report of runs."""
