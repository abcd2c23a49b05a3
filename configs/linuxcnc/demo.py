"""tools/linuxcnc-demo: the five_axis_ac program under LinuxCNC with compensation off, through
chaincomp-lcm-bridge (chaincompd), through chaincomp_rt, and with LinuxCNC's own per-joint
compensation files and matrixkins' matrix written by `chaincomp export` (no daemon; matrixkins
where this LinuxCNC has it), and the tool-point error the
simulated true machine makes along the path: max and RMS at the dwells and in motion, the
bridge's lag, the realtime component's cost, the comp files' measured error against the
exporter's prediction, and a plot. With --probing: sphere probing end to end instead
(configs/linuxcnc/probing.py): plan, LinuxCNC probes the simulated true machine, fit,
chaincomp_rt with the fitted params, probe again; the dispersion of both probings."""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

import cnc

MACHINE = os.path.join(cnc.ROOT, "configs", "machines", "five_axis_ac.yaml")
PARAMS = os.path.join(cnc.ROOT, "configs", "params", "five_axis_ac-demo.yaml")
LABELS = {"off": "compensation off", "bridge": "chaincomp-lcm-bridge + chaincompd", "rt": "chaincomp_rt",
          "comp": "COMP_FILE tables (chaincomp export)", "matrixkins": "matrixkins (chaincomp export), C at 0"}
PROGRAM = os.path.join(cnc.HERE, "five_axis_ac", "program.ngc")
CHAINCOMP = os.path.join(cnc.ROOT, ".venv", "bin", "chaincomp")


def say(text: str) -> None:
    print(f"linuxcnc-demo: {text}", file=sys.stderr, flush=True)


def export_tables(folder: str) -> dict[int, str]:
    """The demo params as LinuxCNC compensation files, through the CLI as a user writes them."""
    say("writing LinuxCNC compensation files: chaincomp export --format linuxcnc-comp")
    report = subprocess.run([CHAINCOMP, "export", MACHINE, "--params", PARAMS, "--format", "linuxcnc-comp",
                             "-o", folder, "--no-breakdown", "--json"], stdout=subprocess.PIPE, text=True, check=True)
    names = [j["axis"] for j in json.loads(report.stdout)["joints"]]
    return {n: os.path.join(folder, f"joint{n}_{a}.comp") for n, a in enumerate(names)}


def predicted_at_dwells(run, machine, params, files: dict[int, str]) -> np.ndarray:
    """What chaincomp's model of the exported tables says the tool error is at each dwell
    (the tables read back from the files; LinuxCNC's rule: linear, held outside, float trims)."""
    from chaincomp.analysis import export as X
    from chaincomp.cli.common import values_for

    values, _ = values_for(machine, PARAMS, [])
    exact = X.ExactModel(machine)
    tables = []
    for n, a in enumerate(machine.axes):
        rows = np.loadtxt(files[n], ndmin=2)
        tables.append(X.JointTable(a, rows[:, 0], rows[:, 1], rows[:, 2]))
    out = []
    for s in cnc.dwells(run.pos_commands)[1:]:
        q = cnc.to_internal(machine, run.pos_commands[s])
        measured, _ = cnc.tool_errors(machine, params, run.pos_commands[s], run.drives[s])
        predicted = X.tool_error(exact, values, q, X.apply_tables(tables, q)).T
        out.append(np.abs(measured - predicted).max())
    return np.array(out)


def export_matrixkins(folder: str) -> tuple[str, np.ndarray]:
    """The demo params as matrixkins' C_xx..C_zz, through the CLI: the HAL file and C."""
    say("writing matrixkins parameters: chaincomp export --format linuxcnc-matrixkins")
    path = os.path.join(folder, "matrixkins.hal")
    report = subprocess.run([CHAINCOMP, "export", MACHINE, "--params", PARAMS, "--format", "linuxcnc-matrixkins",
                             "-o", path, "--no-breakdown", "--json"], stdout=subprocess.PIPE, text=True, check=True)
    return path, np.array(json.loads(report.stdout)["matrix"])


def matrixkins_programmed(run, c: np.ndarray) -> np.ndarray:
    """The programmed axes along a matrixkins run: its forward kinematics, C^-1 . joints on X,
    Y, Z (the rest passed through)."""
    out = run.pos_commands.copy()
    out[:, :3] = np.linalg.solve(c, out[:, :3].T).T
    return out


def install_rt() -> None:
    say("building chaincomp_rt for five_axis_ac with the demo params")
    out = subprocess.run([CHAINCOMP, "build", "--linuxcnc", MACHINE, "--params", PARAMS],
                         stdout=subprocess.PIPE, text=True, check=True).stdout.split()[0]
    if os.geteuid() == 0:
        subprocess.run([CHAINCOMP, "build", "--linuxcnc", MACHINE, "--params", PARAMS, "--install"],
                       stdout=subprocess.DEVNULL, check=True)
    else:
        say("installing it into /usr/lib/linuxcnc/modules (sudo)")
        subprocess.run(["sudo", "install", "-m", "644", out, "/usr/lib/linuxcnc/modules/chaincomp_rt.so"], check=True)


def stats(values: np.ndarray) -> dict:
    return {"max": float(values.max()), "rms": float(np.sqrt(np.mean(values ** 2)))} if len(values) else {}


def summarize(run, machine, params, programmed=None) -> dict:
    # the program's joint commands (joint.N.pos-cmd): on the comp route LinuxCNC's trims
    # come after them, in motor-pos-cmd; on the others the two are equal (matrixkins: the
    # programmed axes are its forward kinematics of them, `programmed`)
    found = cnc.dwells(run.pos_commands)
    if run.returncode != 0 or len(found) < 2:
        raise SystemExit(f"linuxcnc-demo: the run in {run.work} failed:\n{run.log[-2000:]}")
    point, _ = cnc.tool_errors(machine, params, run.pos_commands if programmed is None else programmed, run.drives)
    err_um = np.linalg.norm(point, axis=1) * 1e3
    program = np.zeros(len(err_um), bool)
    # from the first dwell on: the move there leaves A = 0 at home, a singular pose (the tool
    # along C), where the rate limit spreads a large C correction over a few hundred ms
    program[found[1].start:] = True
    at_dwell = np.zeros(len(err_um), bool)
    for s in found[1:]:
        at_dwell[s] = True
    out = {"periods": int(program.sum()), "dwells_um": stats(err_um[at_dwell]),
           "motion_um": stats(err_um[program & ~at_dwell]), "t": (np.arange(len(err_um)) - found[0].stop) * 1e-3,
           "error_um": err_um}
    extra = (run.lag_ms if run.route == "bridge" else run.samples[:, cnc.COL_COST])[program] \
        if run.route in ("bridge", "rt") else None
    return out, extra


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="tools/linuxcnc-demo", description=__doc__)
    p.add_argument("--plot", default=os.path.join(cnc.ROOT, "out", "linuxcnc-demo.png"), metavar="OUT.png",
                   help="where the plot goes (default out/linuxcnc-demo.png)")
    p.add_argument("--routes", help="comma list of off, bridge, rt, comp, matrixkins (default all; matrixkins "
                                    "only where this LinuxCNC has it: 2.10 and later)")
    p.add_argument("--format", choices=("text", "json"), default="text", help="output format (default text)")
    p.add_argument("--probing", action="store_true",
                   help="sphere probing instead: probe plan, LinuxCNC probes the simulated true machine, probe fit, "
                        "chaincomp_rt with the fitted params, probe again (about 4 minutes)")
    args = p.parse_args(argv)
    reason = cnc.unavailable()
    if reason:
        raise SystemExit(f"linuxcnc-demo: {reason}")
    if args.probing:
        import probing

        r = probing.route()
        print(json.dumps(r) if args.format == "json" else probing.report(r))
        return 0
    no_matrixkins = cnc.matrixkins_unavailable()
    if args.routes is None:
        routes = [r for r in cnc.ROUTES if r != "matrixkins" or not no_matrixkins]
        if no_matrixkins:
            say(f"no matrixkins route: {no_matrixkins}")
    else:
        routes = args.routes.split(",")
    for r in routes:
        if r not in cnc.ROUTES:
            p.error(f"--routes: unknown route {r!r} (expected {', '.join(cnc.ROUTES)})")
    if "matrixkins" in routes and no_matrixkins:
        p.error(f"--routes matrixkins: {no_matrixkins}")
    from chaincomp import load_machine, load_params

    machine, params = load_machine(MACHINE), None
    params = load_params(PARAMS, machine)
    if "rt" in routes:
        install_rt()
    results = {}
    for r in routes:
        say(f"running the program: {LABELS[r]}")
        comp = export_tables(tempfile.mkdtemp(prefix="chaincomp-demo-comp-")) if r == "comp" else None
        if r == "matrixkins":
            hal, c = export_matrixkins(tempfile.mkdtemp(prefix="chaincomp-demo-matrixkins-"))
            with open(PROGRAM) as f:
                program = cnc.without_c_moves(f.read())
            run = cnc.run(r, matrixkins=hal, program=program)
            summary, extra = summarize(run, machine, params, matrixkins_programmed(run, c))
            from chaincomp.cli.common import values_for

            values, _ = values_for(machine, PARAMS, [])
            _, off = cnc.matrixkins_at_dwells(run, machine, params, values, c, program)
            summary["measured_minus_predicted_um"] = off * 1e3
            # the same program (C at 0) without compensation: the baseline this route compares with
            programmed = matrixkins_programmed(run, c)
            uncompensated, _ = cnc.tool_errors(machine, params, programmed, programmed)
            keep = np.zeros(len(programmed), bool)
            keep[cnc.dwells(run.pos_commands)[1].start:] = True
            summary["off_same_program_um"] = stats(np.linalg.norm(uncompensated[keep], axis=1) * 1e3)
        else:
            run = cnc.run(r, comp=comp)
            summary, extra = summarize(run, machine, params)
        if comp:
            summary["measured_minus_predicted_um"] = float(predicted_at_dwells(run, machine, params, comp).max() * 1e3)
        if r == "bridge":
            summary["lag_ms"] = dict(zip(("p50", "p99", "max"), map(float, np.percentile(extra, [50, 99, 100]))))
        if r == "rt":
            summary["cost_ns"] = dict(zip(("p50", "p99", "max"), map(float, np.percentile(extra, [50, 99, 100]))))
            # the baseline in the same periods: LinuxCNC's motion controller (HAL's .time, CPU clocks)
            start = cnc.dwells(run.commands)[1].start
            ours, motion = run.samples[start:, cnc.COL_RT_CLOCKS], run.samples[start:, cnc.COL_MC_CLOCKS]
            summary["clocks"] = {"chaincomp_rt_p50": float(np.median(ours)), "motion_controller_p50": float(np.median(motion)),
                                 "ratio_p50": float(np.median(ours) / np.median(motion)),
                                 "ratio_p99": float(np.percentile(ours, 99) / np.percentile(motion, 99))}
        results[r] = summary
    hardware = f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {platform.release()}"
    try:
        with open("/proc/cpuinfo") as f:
            hardware = next(ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")) + \
                f", {os.cpu_count()} CPUs"
    except (OSError, StopIteration):
        pass
    if args.format == "json":
        print(json.dumps({"hardware": hardware, "routes": {r: {k: v for k, v in s.items() if k not in ("t", "error_um")}
                                                           for r, s in results.items()}}))
    else:
        print(f"five_axis_ac under LinuxCNC (trivkins; matrixkins on its route; 1 ms servo period, POSIX non-realtime); {hardware}")
        print("tool-point error of the simulated true machine (exact model, demo params), um, from the first "
              "dwell on (the move there leaves the singular pose A = 0):")
        print(f"  {'route':36s} {'dwells max':>11s} {'RMS':>9s} {'motion max':>11s} {'RMS':>9s}")
        for r, s in results.items():
            print(f"  {LABELS[r]:36s} {s['dwells_um']['max']:11.4f} {s['dwells_um']['rms']:9.4f} "
                  f"{s['motion_um']['max']:11.4f} {s['motion_um']['rms']:9.4f}")
        if "bridge" in results:
            lag = results["bridge"]["lag_ms"]
            print(f"bridge lag (age of the applied correction): p50 {lag['p50']:.2f} ms, p99 {lag['p99']:.2f} ms, "
                  f"max {lag['max']:.2f} ms")
        if "comp" in results:
            print(f"COMP_FILE tables: measured minus chaincomp export's prediction at the dwells, largest "
                  f"{results['comp']['measured_minus_predicted_um']:.6f} um")
        if "matrixkins" in results:
            m = results["matrixkins"]
            print(f"matrixkins: measured minus chaincomp export's prediction at the dwells, largest "
                  f"{m['measured_minus_predicted_um']:.6f} um; its program holds C at 0, and without "
                  f"compensation that program's error is max {m['off_same_program_um']['max']:.4f} um, "
                  f"RMS {m['off_same_program_um']['rms']:.4f} um")
        if "rt" in results:
            c = results["rt"]["cost_ns"]
            print(f"chaincomp_rt cost per servo period: p50 {c['p50']:.0f} ns, p99 {c['p99']:.0f} ns, "
                  f"max {c['max']:.0f} ns")
            k = results["rt"]["clocks"]
            print(f"  against LinuxCNC's motion-controller in the same periods (CPU clocks): p50 "
                  f"{k['chaincomp_rt_p50']:.0f} / {k['motion_controller_p50']:.0f} = {k['ratio_p50']:.2f}, "
                  f"p99 ratio {k['ratio_p99']:.2f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    for r, s in results.items():
        keep = s["t"] >= 0
        ax.semilogy(s["t"][keep], np.maximum(s["error_um"][keep], 1e-6), label=LABELS[r], lw=1)
    ax.set_xlabel("time into the program, s")
    ax.set_ylabel("tool-point error, um")
    ax.set_title("five_axis_ac under LinuxCNC: actual minus programmed tool point")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    os.makedirs(os.path.dirname(os.path.abspath(args.plot)), exist_ok=True)
    fig.savefig(args.plot, dpi=120, bbox_inches="tight")
    say(f"plot: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
