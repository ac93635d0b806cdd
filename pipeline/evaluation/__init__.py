"""Evaluation of every method on shared test scenarios, and the statistics of the report."""
