"""Answers about a machine: the error budget and tolerances, formula checks, the report, lint.
Depends on chaincomp.model and chaincomp.symbolic."""
