"""Write docs/reference/commands.md from every installed command's --help (run from the repo):

    python docs/tools/write_commands_reference.py

tests/test_docs.py checks that the page names every option each --help lists.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "reference" / "commands.md"
COMMANDS = [("am-run",), ("am-trials",), ("am-vehicle",), ("am-demo",), ("simulator",), ("companion",),
            ("ground-station",), ("ground-station", "record"), ("ground-station", "review"), ("ground-station", "keys")]
INTRO = "# Commands\n\nEvery command the package installs, with its options and exit codes, as its `--help` prints\nthem (this page is written by `python docs/tools/write_commands_reference.py`). All of them share one convention for exit codes:\n\n| code | meaning |\n|---|---|\n| 0 | success (for `am-trials`: the campaign ran, whatever its success rate) |\n| 1 | a link or process failure: a peer that does not answer, a process that died, a trial that raised |\n| 2 | bad configuration or arguments: the message names the file and key, or the flag, and what was wrong |\n| 3 | scenario mismatch: a companion and the simulator were given different scenarios (`companion`) |\n| 4 | the mission failed: the verdict names the criterion missed and when (`am-run`, `simulator`) |\n| 130 | interrupted by SIGINT (Ctrl-C) or SIGTERM (`am-run`, `simulator`, `am-trials`); a companion or recorder stopped by a signal ends cleanly with 0, as a supervisor expects |\n\nWhich command to reach for:\n\n| command | what it does | guide |\n|---|---|---|\n| `am-run` | a whole run on one host: the simulator, one companion per AM, the recorder, the review | [run N AMs](../guides/run_n_ams.md) |\n| `am-trials` | a campaign of randomized trials, locally or on a Dask cluster | [campaigns](../guides/campaigns.md) |\n| `am-vehicle` | a vehicle's thrust margin and torque authority | [vehicles](../vehicles.md) |\n| `am-demo` | one AM in free flight under the paper's law, no processes | [architecture](../architecture.md) |\n| `simulator`, `companion`, `ground-station` | the processes `am-run` starts, for running them by hand | [by hand across hosts](../guides/by_hand.md) |\n\n"


def main() -> int:
    env = {**os.environ, "COLUMNS": "100", "PYTHONPATH": str(ROOT)}
    bindir = str(Path(sys.executable).parent)
    parts = [INTRO]
    for argv in COMMANDS:
        exe = shutil.which(argv[0], path=bindir) or shutil.which(argv[0])
        text = subprocess.run([exe, *argv[1:], "--help"], capture_output=True, text=True, env=env, check=True).stdout
        parts.append(f"## `{' '.join(argv)}`\n\n```text\n{text.rstrip()}\n```\n\n")
    PAGE.write_text("".join(parts).rstrip() + "\n")
    print(PAGE)
    return 0


if __name__ == "__main__":
    sys.exit(main())
