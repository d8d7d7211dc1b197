"""What the A/B benchmarks share: another revision's code in a worktree, and a driver run in it.

``render_throughput.py`` and ``bake_throughput.py`` time the working tree against a git revision,
each side in a process of its own running a small driver script (a string, so that it runs
inside the measured revision's tree). The driver prints its result as one ``RESULT {json}`` line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def revision_tree(rev: str, root: Path, tool: str) -> tuple[Path, str]:
    """A detached worktree of ``rev`` under ``root`` (made once, reused): its path and full hash."""
    sha = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--verify", f"{rev}^{{commit}}"], capture_output=True, text=True
    )
    if sha.returncode:
        sys.exit(f"{tool}: --against {rev!r} is not a commit of this repository")
    full = sha.stdout.strip()
    tree = root / f"rev-{full[:12]}" / "code"
    if not (tree / ".git").exists():
        tree.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), full], check=True)
    return tree, full


def run_driver(driver: str, code_root: Path, payload: dict, tool: str, *, verbose: bool = False) -> dict:
    """``driver`` run with ``code_root``'s package first on the path and ``payload`` as its argument:
    the dict of its ``RESULT`` line (its other output echoed when ``verbose``)."""
    path = os.pathsep.join(filter(None, [str(code_root), os.environ.get("PYTHONPATH")]))
    proc = subprocess.run(
        [sys.executable, "-c", driver, json.dumps(payload)],
        cwd=code_root,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
    )
    if verbose:
        sys.stdout.write("".join(line + "\n" for line in proc.stdout.splitlines() if not line.startswith("RESULT ")))
    if proc.returncode:
        sys.exit(f"{tool}: the run in {code_root} failed:\n{proc.stderr[-4000:]}")
    line = next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])
