"""Numerical routines the model needs on its small paths, in plain Python so that a
single trial, an environment or an agent program does not import scipy for them: the
exact assignment solver (`lsap`, scipy's `linear_sum_assignment` with its ties) and
chi-square quantiles (`chisquare`). They import numpy, and scipy only where it pays.
Beside them, the arrays a run reuses across its cycles (`buffers`), and how an estimate
is coded for the radio, conservatively when quantized (`codec`)."""
