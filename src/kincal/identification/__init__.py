"""Identification: parameters, rank-revealing selection, solver, penalty, CV, results."""
