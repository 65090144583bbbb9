"""Human-readable preflight report: violations first (by line), then the summary."""

from __future__ import annotations

from cdprhost.preflight.report import PreflightReport


def format_duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def render_text(report: PreflightReport, *, max_rows: int = 20) -> str:
    lines: list[str] = []
    verdict = "OK" if report.ok else f"{report.violations_total} violation(s)"
    lines.append(f"preflight of {report.source} with profile {report.profile}: {verdict}")
    if report.violations:
        lines.append(f"  {'line':>7}  {'rule':<16} {'point (machine mm)':<28} detail")
        for v in report.violations[:max_rows]:
            pt = "({:.2f}, {:.2f}, {:.2f})".format(*v.point)
            lines.append(f"  {v.line:>7}  {v.rule:<16} {pt:<28} {v.detail}")
        hidden = report.violations_total - min(len(report.violations), max_rows)
        if hidden > 0:
            by_rule = ", ".join(f"{k}: {n}" for k, n in sorted(report.violations_by_rule.items()))
            lines.append(f"  ... {hidden} more not shown ({by_rule})")
    lines.append(
        f"summary: {report.moves} moves, {report.layers} layers, filament {report.filament_mm:.1f} mm, "
        f"estimated time {format_duration(report.estimated_time_s)} ({report.estimated_time_s:.1f} s), "
        f"{report.moves_slowed_by_modules} moves slowed by module limits"
    )
    if report.print_box_gcode is not None:
        b = report.print_box_gcode
        lines.append(
            f"printed part (G-code frame): x {b.min[0]:.2f}..{b.max[0]:.2f}, y {b.min[1]:.2f}..{b.max[1]:.2f}, z {b.min[2]:.2f}..{b.max[2]:.2f} mm"
        )
    if report.notes:
        notes = ", ".join(f"{n.word} x{n.count} (first at line {n.line})" for n in report.notes)
        lines.append(f"skipped harmless commands: {notes}")
    return "\n".join(lines)
