"""Calibration: measurement protocols and pose designs, simulated measurements, identification
of the errors, ISO 230-2 laser runs, the ballbar, commanded toolpaths for logs. Depends on
chaincomp.model and chaincomp.symbolic."""
