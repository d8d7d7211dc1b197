"""The validator's report (:mod:`eden_pipe.tools.validate`): failures, checks run and not run, figures."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Report:
    failures: list[tuple[str, str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    rows: int = 0
    files: int = 0
    checks: dict[str, int] = field(default_factory=dict)
    # A check that could not run: (check, reason) -> rows. Printed, never silent.
    not_run: dict[tuple[str, str], int] = field(default_factory=dict)
    # Table columns the dataset does not write (manifest column absent or empty on every row checked).
    absent: list[str] = field(default_factory=list)
    # Measured figures worth a line of their own (the geometry check's agreement per garden).
    notes: list[str] = field(default_factory=list)
    # With wind: per-pixel flow errors (px) of rigid and moving pixels, and the moving ones' distance
    # from the static reprojection, collected over the rows checked (printed as medians and 95th percentiles).
    motion: dict[str, list] = field(default_factory=dict)
    seconds: float = 0.0

    def fail(self, path, check: str, detail: str = "") -> None:
        self.failures.append((str(path), check, detail))

    def ran(self, check: str, n: int = 1) -> None:
        self.checks[check] = self.checks.get(check, 0) + n

    def cannot_run(self, check: str, reason: str) -> None:
        self.not_run[(check, reason)] = self.not_run.get((check, reason), 0) + 1

    def warn(self, message: str) -> None:
        if message not in self.warnings:
            self.warnings.append(message)

    @property
    def ok(self) -> bool:
        return not self.failures

    def motion_line(self) -> str:
        """The wind's flow figures (see ``motion``)."""
        parts = []
        for name, words in (
            ("rigid", "rigid px vs depth reprojection"),
            ("moving", "moving px vs reprojection of the moved point"),
            ("moving_vs_static", "moving px apart from the static reprojection"),
        ):
            values = np.concatenate(self.motion.get(name, [np.zeros(0, np.float32)]))
            if len(values):
                p50, p95 = np.percentile(values, [50, 95])
                parts.append(f"{words}: median {p50:.3g}, p95 {p95:.3g} px ({len(values)} px)")
        return "wind flow: " + "; ".join(parts)

    def lines(self) -> list[str]:
        out = [f"FAIL {path}: {check}" + (f": {detail}" if detail else "") for path, check, detail in self.failures]
        out += [f"WARN {w}" for w in self.warnings]
        out += self.notes
        if self.motion:
            out.append(self.motion_line())
        bad = len({p for p, _, _ in self.failures})
        rate = self.rows / self.seconds if self.seconds > 0 else float("inf")
        ran = ", ".join(f"{k} {v}" for k, v in sorted(self.checks.items()))
        out.append(
            f"validate: {self.rows} rows, {self.files} files, {len(self.failures)} failures in {bad} files "
            f"({self.seconds:.1f} s, {rate:.2f} rows/s); checks: {ran}"
        )
        if self.absent:
            out.append(f"not written: {', '.join(self.absent)} (render.modalities; their checks cannot run)")
        out += [f"not run: {check} on {n} rows: {reason}" for (check, reason), n in sorted(self.not_run.items())]
        out.append("OK" if self.ok else "FAILED")
        return out
