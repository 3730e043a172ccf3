"""The limits of what one command runs, refused before any work: a module of constants
that the command line reads without loading the model."""

__all__ = ["MAX_TRIALS"]

MAX_TRIALS = 100_000
"""The most trials an experiment runs per configuration and method: 10,000 result files
of 10 trials, and about 12 hours of one core at 500 steps. A larger count is refused
before any job is planned."""
