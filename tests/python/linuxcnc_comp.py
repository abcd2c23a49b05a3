"""An independent reader of LinuxCNC's per-joint compensation files ([JOINT_n]COMP_FILE),
written for the tests of chaincomp export from LinuxCNC's source (linuxcnc/linuxcnc, 2.9):

- src/emc/motion/usrmotintf.cc usrmotLoadComp: each line is read as three numbers
  ("%lf %lf %lf"); reading stops at the first line that is not; type 0 lines are
  "nominal, position reached moving forward, moving in reverse" and become the trims
  nominal - position; type 1 lines are "nominal, forward trim, reverse trim";
- src/emc/motion/command.c EMCMOT_SET_JOINT_COMP: at most EMCMOT_COMP_SIZE = 256 entries
  (motion.h), nominals strictly increasing, trims stored as float;
- src/emc/motion/control.c compute_screw_comp: the trim at the commanded position is linear
  between neighbouring entries and the end entries' trims outside them (forward while the
  joint moves forward, reverse while it moves back).
"""

import re

import numpy as np

_TRIPLET = re.compile(r"\s*(\S+)\s+(\S+)\s+(\S+)")
COMP_SIZE = 256


def read(text: str, file_type: int) -> np.ndarray:
    """(entries, 3): nominal, forward trim, reverse trim (float trims), as LinuxCNC loads them."""
    rows = []
    for line in text.splitlines():
        m = _TRIPLET.match(line)
        try:
            row = [float(v) for v in m.groups()] if m else None
        except ValueError:
            row = None
        if row is None:
            break            # LinuxCNC stops reading here, without an error
        rows.append(row)
    table = np.array(rows, float).reshape(-1, 3)
    if file_type == 0:
        table[:, 1] = table[:, 0] - table[:, 1]
        table[:, 2] = table[:, 0] - table[:, 2]
    assert len(table) <= COMP_SIZE, "too many compensation entries"
    assert np.all(np.diff(table[:, 0]) > 0), "compensation values must increase"
    table[:, 1:] = table[:, 1:].astype(np.float32)
    return table


def trim(table: np.ndarray, position, forward: bool = True) -> np.ndarray:
    """The trim at ``position`` (the joint's units): linear between entries, held outside."""
    pos = np.asarray(position, float)
    col = 1 if forward else 2
    nom, t = table[:, 0], table[:, col]
    i = np.clip(np.searchsorted(nom, pos, side="right") - 1, 0, len(nom) - 2)
    frac = np.clip((pos - nom[i]) / (nom[i + 1] - nom[i]), 0.0, 1.0)
    return t[i] + frac * (t[i + 1] - t[i])
