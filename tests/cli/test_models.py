"""``rfmap models`` without an optional extra installed (a plain ``pip install .``): the FNO model is listed as
needing ``rfmap[fno]``, exit status 0, no traceback."""
from __future__ import annotations

import subprocess
import sys

import pytest

from rfmap.surrogate import WEIGHTS_DIR, models

#: ``rfmap models`` in a process where ``import neuralop`` fails, as where the package is not installed
WITHOUT_NEURALOP = ("import sys; sys.modules['neuralop'] = None\n"
                    "from rfmap.cli.commands import main\n"
                    "sys.exit(main(sys.argv[1:]))")


def _fno_models() -> list[str]:
    import json

    return [m for m in models()
            if json.loads((WEIGHTS_DIR / f"{m}.json").read_text()).get("model", {}).get("arch") == "fno"]


@pytest.mark.parametrize("extra", [[], ["--lineage"]])
def test_models_without_neuraloperator(extra):
    fno = _fno_models()
    if not fno:
        pytest.skip("no FNO model is shipped")
    proc = subprocess.run([sys.executable, "-c", WITHOUT_NEURALOP, "models", *extra], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr and "Error" not in proc.stderr
    for name in models():  # every model is still listed
        assert name in proc.stdout
    if not extra:
        lines = {ln.split()[0]: ln for ln in proc.stdout.splitlines() if ln.strip()}
        for name in fno:
            assert "needs rfmap[fno]" in lines[name]
        assert not any("needs rfmap" in lines[m] for m in models() if m not in fno)
