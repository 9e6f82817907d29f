"""Optuna studies: search spaces, storages, workers and reports."""
