"""Experiments: conditions x seeds from a spec, run through a study storage, reported the way the thesis does."""
