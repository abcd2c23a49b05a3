"""The package's layers (codegen/.importlinter): cli > analysis | emit | measure > symbolic >
model > errors, and no import cycle inside a package. import-linter reads every import,
including the ones inside functions."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_import_layers_and_no_cycles():
    lint_imports = Path(sys.executable).with_name("lint-imports")
    r = subprocess.run([str(lint_imports), str(ROOT / "codegen/.importlinter")], capture_output=True, text=True,
                       cwd=ROOT / "codegen")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "3 kept, 0 broken" in r.stdout
