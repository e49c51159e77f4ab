"""The packages' layering, as pyproject.toml's [tool.importlinter] contracts state it: the
simulator imports nothing of the companion, amcore imports no adapter, process or runner, and
each package imports only the layers below it (docs/architecture.md). import-linter reads the
imports of every module, the ones inside functions included, without importing any of them."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("importlinter", reason="import-linter is not installed (it is in the test extra: "
                                           "pip install -e '.[test]')")

# lint_imports puts the working directory first on sys.path: the packages of this tree, not an installed copy
LINT = ("import sys; from importlinter.cli import lint_imports; "
        "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")


def test_every_import_contract_is_kept():
    run = subprocess.run([sys.executable, "-c", LINT], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"lint-imports: a contract is broken\n{run.stdout}\n{run.stderr}"
    assert "0 broken" in run.stdout, run.stdout
