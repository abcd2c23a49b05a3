"""The ``chaincomp`` command line: one module per verb."""
