"""The commands that are neither training nor studies: simulate and bench."""
