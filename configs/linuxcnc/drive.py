#!/usr/bin/python3
"""Headless [DISPLAY] program of chaincomp's LinuxCNC configurations: resets estop, switches
the machine on, homes, records every servo period with halsampler (sampler.0), runs
[DISPLAY]OPEN_FILE to its end and exits, which shuts LinuxCNC down. Debian's python3 (the
linuxcnc module lives there). Environment, set by cnc.py:
  CHAINCOMP_SAMPLES   file for halsampler's rows (default samples.txt)
  CHAINCOMP_EVENTS    file for the driver's own timeline (JSON lines; default events.txt)
  CHAINCOMP_SETTLE_S  seconds to wait after homing (the correction ramps in), default 1.0
  CHAINCOMP_AT_S      'SECONDS:COMMAND' run with sh that many seconds after the program starts
  CHAINCOMP_TIMEOUT_S how long the program may run, default 60 (a probing program runs longer)
"""
import json
import os
import signal
import subprocess
import sys
import time

import linuxcnc

TIMEOUT_S = float(os.environ.get("CHAINCOMP_TIMEOUT_S", "60"))


def main() -> int:
    ini = linuxcnc.ini(sys.argv[sys.argv.index("-ini") + 1])
    program = os.path.abspath(ini.find("DISPLAY", "OPEN_FILE"))
    events = open(os.environ.get("CHAINCOMP_EVENTS", "events.txt"), "w")

    def event(what, **kw):
        events.write(json.dumps({"t": time.monotonic(), "event": what, **kw}) + "\n")
        events.flush()

    s, c, e = linuxcnc.stat(), linuxcnc.command(), linuxcnc.error_channel()

    def wait(cond, what):
        end = time.monotonic() + TIMEOUT_S
        while time.monotonic() < end:
            s.poll()
            if cond():
                return
            failed(e.poll())
            time.sleep(0.01)
        raise SystemExit(f"drive.py: timed out waiting for {what}")

    def failed(err):
        """An error from LinuxCNC (a G-code error, a limit): record it and stop."""
        if err:
            event("error", text=err[1])
            raise SystemExit(f"drive.py: LinuxCNC: {err[1]}")

    wait(lambda: s.task_state != 0, "the task")
    c.state(linuxcnc.STATE_ESTOP_RESET)
    c.state(linuxcnc.STATE_ON)
    wait(lambda: s.task_state == linuxcnc.STATE_ON, "machine on")
    c.mode(linuxcnc.MODE_MANUAL)
    c.wait_complete()
    c.home(-1)
    wait(lambda: all(s.homed[i] for i in range(s.joints)), "homing")
    sampler = subprocess.Popen(["halsampler", "-t"], stdout=open(os.environ.get("CHAINCOMP_SAMPLES", "samples.txt"), "w"))
    event("homed")
    time.sleep(float(os.environ.get("CHAINCOMP_SETTLE_S", "1.0")))
    c.mode(linuxcnc.MODE_AUTO)
    c.wait_complete()
    c.program_open(program)
    c.auto(linuxcnc.AUTO_RUN, 0)
    event("run", program=program)
    wait(lambda: s.interp_state != linuxcnc.INTERP_IDLE, "the program to start")
    at = os.environ.get("CHAINCOMP_AT_S", "")
    pending = [(float(at.split(":", 1)[0]), at.split(":", 1)[1])] if at else []
    start = time.monotonic()
    end = start + TIMEOUT_S
    while time.monotonic() < end:
        s.poll()
        if pending and time.monotonic() - start >= pending[0][0]:
            event("at", command=pending[0][1])
            subprocess.run(["sh", "-c", pending.pop()[1]])
        failed(e.poll())
        if s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0:
            break
        time.sleep(0.005)
    else:
        raise SystemExit("drive.py: the program did not finish")
    time.sleep(0.2)  # the last dwell's tail in the record
    event("done")
    sampler.send_signal(signal.SIGTERM)
    sampler.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
