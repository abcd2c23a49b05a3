"""The machine as the user writes it: YAML source with line numbers, units, the expression
language of lengths and limits, the machine file (links, axes, constants, errors), error values
that vary along an axis, params files, URDF and DH import. Depends on nothing above it."""
