"""Datasets: simulators and readers that produce sequences for the models."""
