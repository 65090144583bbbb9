"""Human-readable preflight report: violations first (by line), then the summary."""

from __future__ import annotations

from cdprhost.preflight.report import PreflightReport


def format_duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _pct(ours: float, theirs: float) -> str:
    return f"{100.0 * (ours - theirs) / theirs:+.2f} %" if theirs else "n/a"


def render_text(report: PreflightReport, *, max_rows: int = 20) -> str:
    lines: list[str] = []
    verdict = "OK" if report.ok else f"{report.violations_total} violation(s)"
    lines.append(f"preflight of {report.source} with profile {report.profile}: {verdict}")
    if report.violations:
        lines.append(f"  {'line':>7}  {'rule':<18} {'point (machine mm)':<28} detail")
        for v in report.violations[:max_rows]:
            pt = "({:.2f}, {:.2f}, {:.2f})".format(*v.point)
            where = "start" if v.line == 0 else str(v.line)
            lines.append(f"  {where:>7}  {v.rule:<18} {pt:<28} {v.detail}")
        hidden = report.violations_total - min(len(report.violations), max_rows)
        if hidden > 0:
            by_rule = ", ".join(f"{k}: {n}" for k, n in sorted(report.violations_by_rule.items()))
            lines.append(f"  ... {hidden} more not shown ({by_rule})")
    if report.warnings:
        lines.append(
            f"warnings ({report.warnings_total}; skipped when printing, --strict makes them errors):"
        )
        for w in report.warnings[:max_rows]:
            more = f" and {w.count - len(w.lines)} more" if w.count > len(w.lines) else ""
            at = ", ".join(str(n) for n in w.lines[:8])
            what = "unknown command" if w.kind == "unknown_command" else "ignored parameters"
            text = f" ({w.text})" if w.text and w.text != w.word else ""
            lines.append(f"  {w.word}{text}: {what}, x{w.count} at line {at}{more}")
    lines.append(
        f"summary: {report.moves} moves, {report.layers} layers, filament {report.filament_mm:.1f} mm, "
        f"estimated time {format_duration(report.estimated_time_s)} ({report.estimated_time_s:.1f} s), "
        f"{report.moves_slowed_by_modules} moves slowed by module limits"
    )
    lines.extend(_board(report))
    s = report.slicer
    if s is not None and (s.filament_mm is not None or s.time_s is not None):
        parts = []
        if s.filament_mm is not None:
            parts.append(
                f"filament {s.filament_mm:.1f} mm (ours {_pct(report.filament_mm, s.filament_mm)})"
            )
        if s.time_s is not None:
            target = (
                f"with the limits of the printer exported from profile '{s.exported_profile}'"
                if s.exported_profile
                else "for its own printer"
            )
            parts.append(
                f"time {format_duration(s.time_s)} {target} (ours "
                f"{format_duration(report.estimated_time_s)}, "
                f"{_pct(report.estimated_time_s, s.time_s)})"
            )
        lines.append(f"the slicer ({s.slicer}) says: " + ", ".join(parts))
    if report.print_box_gcode is not None:
        b = report.print_box_gcode
        lines.append(
            f"printed part (G-code frame): x {b.min[0]:.2f}..{b.max[0]:.2f}, y {b.min[1]:.2f}..{b.max[1]:.2f}, z {b.min[2]:.2f}..{b.max[2]:.2f} mm"
        )
    lines.extend(_placement(report))
    if report.retarget is not None:
        r = report.retarget
        blocks = []
        if r.start_lines:
            blocks.append(f"start lines {r.start_lines[0]}-{r.start_lines[1]}")
        if r.end_lines:
            blocks.append(f"end lines {r.end_lines[0]}-{r.end_lines[1]}")
        temps = f"hotend {r.hotend_c:g} C, bed {r.bed_c:g} C"
        lines.append(
            f"retargeted: replaced {' and '.join(blocks) or 'nothing'} (found by {r.found_by}) "
            f"by the profile's start/end G-code ({temps})"
        )
        if r.replaced:
            lines.append(f"  replaced commands: {', '.join(r.replaced)}")
        if r.purge_lines:
            lines.append(
                f"  replaced purge lines (start G-code without slicer markers): "
                f"{'; '.join(r.purge_lines)}"
            )
    if report.objects:
        cancelled = (
            f"; cancelled: {', '.join(report.cancelled_objects)}"
            if report.cancelled_objects
            else ""
        )
        labels = report.object_labels
        named = [f'{o} "{labels[o]}"' if labels.get(o) else o for o in report.objects]
        lines.append(
            f"objects ({len(named)}; --cancel-object NAME skips one): {', '.join(named)}{cancelled}"
        )
    if report.notes:
        notes = ", ".join(f"{n.word} x{n.count} (first at line {n.line})" for n in report.notes)
        lines.append(f"skipped harmless commands: {notes}")
    return "\n".join(lines)


def advice(report: PreflightReport) -> list[str]:
    """Where the part is and how to move it (placement lines of the text report)."""
    return _placement(report)


NO_FIT = "no offset fits the part in the workspace"


def shift_text(offset: tuple[float, float]) -> str:
    """The X/Y shift applied to a file, as the reports say it."""
    return f"shifted by X {offset[0]:+.2f}, Y {offset[1]:+.2f} mm"


def offset_option(offset: tuple[float, float]) -> str:
    """The ``--offset`` that applies ``offset``."""
    return f"--offset {offset[0]:g},{offset[1]:g}"


def _placement(report: PreflightReport) -> list[str]:
    p = report.placement
    if p is None:
        return []
    out = []
    if p.offset != (0.0, 0.0):
        out.append(f"placement: {shift_text(p.offset)}")
    if p.allowed is not None and p.part_min is not None and p.part_max is not None:
        a = p.allowed
        out.append(
            f"part (from the first layer on): x {p.part_min[0]:.2f}..{p.part_max[0]:.2f}, "
            f"y {p.part_min[1]:.2f}..{p.part_max[1]:.2f} mm; allowed at z {a.z:.1f} (its worst "
            f"height): x {a.x[0]:.1f}..{a.x[1]:.1f}, y {a.y[0]:.1f}..{a.y[1]:.1f} mm (a triangle)"
        )
        if p.fit_offset is not None:
            out.append(f"  the part fits with {offset_option(p.fit_offset)}")
        else:
            out.append(f"  {NO_FIT}")
    hint = start_block_hint(report)
    if hint:
        out.append(hint)
    return out


def start_block_hint(report: PreflightReport) -> str | None:
    """A hint when moves before the first layer (another printer's start block) fail."""
    if report.retarget is not None or not report.violations:
        return None
    firsts = [
        v.line for v in report.violations if v.rule in ("build_volume", "tension", "slider_travel")
    ]
    if not firsts or report.layers == 0:
        return None
    return (
        "  if the file was sliced for another printer, --retarget replaces its start and end "
        "blocks by this machine's and centres the part"
    )


def _board(report: PreflightReport) -> list[str]:
    """The board the estimate is for, and what it costs when it slows the print."""
    b = report.board
    if b is None:
        return []
    where = "as it announced" if b.source == "device" else "the profile's [device] record"
    if b.message:
        return [f"board: {b.message} ({where})"]
    return [f"board: {b.max_step_rate:,} steps/s ({where}) does not slow this print"]
