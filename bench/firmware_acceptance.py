"""Issue 29's tables for its closing note: the acceptance rows, pass or fail, and the rate
searches engine beside engine.

- `--acceptance`: exactly the issue's acceptance rows (the rates at their figures on a
  build announcing them, the cup, the estimate, the 30 s streams, heaters off, flash,
  RAM and stack), pass or fail, as a table for the closing note.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import firmware_measure as measure
import firmware_rates as rates_bench

#: an acceptance row: what, the issue's figure, measured, passed (None: not run)
Row = tuple[str, str, str, bool | None]


def rates_table(searches: list[dict[str, Any]]) -> list[str]:
    """The rate searches of one run as one markdown table, engine beside engine."""
    head: tuple[str, ...] = (
        "configuration",
        "engine",
        "highest R (steps/s)",
        "worst / p99 edge at R",
    )
    head += ("ISR load at R", "first fail")
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for i, config in enumerate(rates_bench.CONFIGS):
        for search in searches:
            r = search["highest_rate"][i]
            rate = f"{r['rate']:,}" if r.get("rate") else "none"
            edge = f"{r['worst_us']} / {r['p99_us']} us" if "worst_us" in r else ""
            load = f"{r['isr_load_pct_of_motion']} %" if "isr_load_pct_of_motion" in r else ""
            fail = f"{r['lowest_fail']:,}: {r['fail_reason']}" if "lowest_fail" in r else "none"
            lines.append(f"| {config} | {search['engine']} | {rate} | {edge} | {load} | {fail} |")
    for search in searches:
        ramp = search.get("print_mix_with_ramps_at_its_rate")
        if ramp:
            verdict = "passes" if ramp["passed"] else f"fails: {ramp['fail_reason']}"
            lines.append(
                f"| the mix with ramps from rest to {ramp['rate']:,} and back | "
                f"{search['engine']} | {verdict} | {ramp['worst_us']} / {ramp['p99_us']} us"
                f" | {ramp['isr_load_pct_of_motion']} % | |"
            )
    idle = ", ".join(f"{s['engine']} {s['isr_idle_share_pct']} %" for s in searches)
    lines += ["", f"The step interrupts' share of the CPU with nothing moving: {idle}."]
    return lines


def acceptance_rows(engines: tuple[str, ...] = ("",)) -> list[Row]:
    """The issue's acceptance rows: (what, the issue's figure, measured, passed); the rate
    rows for each engine of ``engines`` (build options: "" the default engine)."""
    rows: list[Row] = []
    for config, rate in (
        ("a print's mix", 30_000),
        ("three modules out of step, extruder running", 33_000),
        ("one module alone", 100_000),
    ):
        rates = rates_bench.rates_of(config, rate)
        for cflags in engines:
            # what the engine takes, not what it announces: 3 x 33,000 + 3,300 is over the
            # budget its axes share (STEP_BUDGET, 80,000), which the build leaves out here
            measured = f"{cflags} -DTOTAL_STEP_RATE=0UL" if "STEP_ENGINE" in cflags else cflags
            build = rates_bench.variant(max(rates), measured)
            p = rates_bench.run_batch(build, rates_bench.constant_batch(rates))
            got = f"worst {p['worst_us']} us, p99 {p['p99_us']} us"
            if not p["passed"]:
                got += f"; {rates_bench.fail_reason(p)}"
            what = f"{config} at R = {rate:,}" + (f" ({build.engine})" if len(engines) > 1 else "")
            rows.append((what, "worst <= 10 us, p99 <= 5 us, clean", got, p["passed"]))
    rate, min_ticks = measure.announced()
    cup = measure.cup(rate, min_ticks)
    rows.append(
        (
            f"cup on the AVR's limits ({rate}/s, {min_ticks} ticks) vs no cap",
            "<= +1 %",
            f"{cup['board_slower_pct']:+.2f} %",
            cup["board_slower_pct"] <= 1.0,
        )
    )
    rows.append(
        (
            "check/print estimate vs the print on the board's limits",
            "within 1 %",
            f"{cup['estimate_error_pct']:+.2f} %",
            abs(cup["estimate_error_pct"]) <= 1.0,
        )
    )
    rows.append(
        (
            "the cup printed on the AVR in simavr equals the Python device's",
            "equal",
            "not run (about 30 min of real time; bench/board_estimate.py's note)",
            None,
        )
    )
    streams = measure.print_like_streams(int(0.9 * rate), rate)
    for name, what in (
        ("clean_2000_per_s", "2,000 segments/s clean, 30 s"),
        ("faults_1000_per_s", "1,000 segments/s, 1e-3 corruption and drop, 30 s"),
    ):
        r = streams[name]
        rows.append(
            (
                f"{what}, print-like at {streams['busiest_module_steps_per_s']}/s",
                "record exact",
                f"exact {r['record_exact']}, {r['host_retransmits']} retx",
                bool(r["record_exact"]),
            )
        )
    worst = max(measure.heaters_off_latencies().values())
    rows.append(
        (
            "heaters off after the watchdog (worst of 4 states)",
            "<= 0.1 s",
            f"{worst:.3f} s",
            worst <= 0.1,
        )
    )
    size, free = measure.size(), measure.stack_free()
    rows.append(
        (
            "flash, RAM, static worst-case stack",
            ">= 64 B stack free",
            f"flash {size['flash_bytes']} B, RAM {size['ram_static_bytes']} B, stack {free} B free",
            free is not None and free >= 64,
        )
    )
    return rows


def print_acceptance(rows: list[Row]) -> None:
    print("| acceptance row | issue | measured | |")
    print("|---|---|---|---|")
    for what, want, got, ok in rows:
        mark = "n/a" if ok is None else ("pass" if ok else "FAIL")
        print(f"| {what} | {want} | {got} | {mark} |")
