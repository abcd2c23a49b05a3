"""identify on the table-table trunnion (ISO 230-7 location errors of A and C): a tracker's
x, y, z at random set-ups, simulated by the numpy product of test_new_machines (written from
the standard, not from chaincomp's chain); the errors an independent rank analysis finds
identifiable are recovered to 1e-9 relative, the others reported and given no value."""

import numpy as np

from chaincomp import load_machine

from helpers import machine_path
from test_identify_any_machine import declared_value, fit_json, injected, in_internal, own_analysis, random_setups, write_csv
from machine_models import trunnion_pose

TRUNNION = machine_path("trunnion_ac")


def trunnion_points(m, axes, errs):
    consts = {s.name: s.to_internal(s.nominal) for s in m.constants}
    rows = len(next(iter(axes.values())))
    out = np.empty((rows, 3))
    for r in range(rows):
        v = dict(consts)
        v.update({k: float(a[r]) for k, a in axes.items()})
        v.update({k: float(np.broadcast_to(e, rows)[r]) for k, e in errs.items()})
        out[r] = trunnion_pose(v)[0]
    return out


def test_identifiable_location_errors_recovered_to_1e9(tmp_path, capsys):
    m = load_machine(TRUNNION)
    declared, axes = random_setups(m, np.random.default_rng(21), 30)
    model = lambda a, e: trunnion_points(m, a, e)  # noqa: E731
    names = [s.name for s in m.errors]
    rank, unident, _ = own_analysis(m, model, axes, names)
    ident = [n for n in names if n not in unident]
    assert ident and rank <= len(names)
    truth = injected(m, np.random.default_rng(22), ident)
    write_csv(tmp_path / "meas.csv", m, declared, model(axes, in_internal(m, truth)))
    doc = fit_json(capsys, TRUNNION, tmp_path / "meas.csv")
    assert set(doc["unidentifiable"]) == unident
    assert set(doc["estimates"]) == set(ident)
    for name in ident:
        assert abs(declared_value(m, doc, name) - truth[name]) <= 1e-9 * abs(truth[name]), name
