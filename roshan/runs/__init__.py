"""Training runs: the loop, collectors, evaluation and reports of run folders."""
