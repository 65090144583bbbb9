"""`cdprhost sim-device`: the simulated firmware on a pseudo-terminal."""

from __future__ import annotations

import argparse
import signal
import sys

from cdprhost.cli.numbers import bounded_float, bounded_int
from cdprhost.cli.options import output_file
from cdprhost.errors import InputError
from firmware_protocol.block_ring import valid_entries
from firmware_protocol.device.config import MAX_SPEEDUP, SimConfig
from firmware_protocol.device.faults import FaultSpec, FaultSpecError
from firmware_protocol.device.firmware import SimDevice
from firmware_protocol.device.pty_server import PtyServer


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "sim-device", help="run the simulated device on a pseudo-terminal (prints its path)"
    )
    p.add_argument(
        "--speedup",
        type=bounded_float(0.0, MAX_SPEEDUP),
        default=1.0,
        metavar="X",
        help="device time runs X times real time",
    )
    p.add_argument(
        "--faults",
        metavar="SPEC",
        default=None,
        help="corrupt=P,drop=P,dup=P,latency_ms=MS,jitter_ms=MS,reset_after=N,stall_after=N,"
        "heater_fail_after=S,thermistor_open_after=S,thermistor_short_after=S,hotend_start_c=C,"
        "seed=N",
    )
    p.add_argument(
        "--record",
        type=output_file,
        metavar="FILE",
        help="JSON lines, one per executed segment, streamed as they execute (flushed on exit)",
    )
    p.add_argument(
        "--firmware",
        choices=("python", "avr"),
        default="python",
        help="python: the device model; avr: the C firmware's ELF in simavr",
    )
    p.add_argument(
        "--max-step-rate",
        type=bounded_int(1, 10_000_000),
        default=None,
        metavar="N",
        help="steps/s per axis the Python device announces and enforces (default "
        f"{SimConfig.max_step_rate}); the AVR firmware announces its own",
    )
    p.add_argument(
        "--profile-step-rate",
        type=bounded_int(1, 10_000_000),
        default=None,
        metavar="N",
        help="steps/s the Python device announces for an axis stepped without a schedule "
        "block (STEPPING; default: the max step rate), as the AVR's step engine announces "
        "its tick's: the host then sends a block for every faster ramp axis",
    )
    p.add_argument(
        "--total-step-rate",
        type=bounded_int(1, 40_000_000),
        default=None,
        metavar="N",
        help="steps/s the Python device takes summed over its four axes (STEP_BUDGET, "
        "protocol 3.3), as the AVR's step engine announces the budget its steppers "
        "share: the host plans under it (default: none beyond each axis's)",
    )
    p.add_argument(
        "--ring-entries",
        type=bounded_int(2, 128),
        default=None,
        metavar="N",
        help="entries of a ring the Python device keeps its schedule blocks in (RING, "
        "protocol 3.2; a power of two), as the AVR's step engine keeps 128: the host then "
        "sends a block only where it fits (default: none, blocks need no room)",
    )
    p.add_argument("--truth", metavar="PROFILE", help="truth machine profile for the virtual mocap")
    p.add_argument("--mocap-dir", metavar="DIR", help="where the virtual mocap writes its takes")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        faults = FaultSpec.parse(args.faults)
    except FaultSpecError as exc:
        raise InputError(str(exc), source="--faults") from None
    if (args.truth is None) != (args.mocap_dir is None):
        given, missing = ("--truth", "--mocap-dir") if args.truth else ("--mocap-dir", "--truth")
        raise InputError(
            f"{given} needs {missing} as well (the virtual mocap needs both)", source=given
        )
    if args.firmware == "avr":
        for given, value in (
            ("--max-step-rate", args.max_step_rate),
            ("--profile-step-rate", args.profile_step_rate),
            ("--ring-entries", args.ring_entries),
            ("--total-step-rate", args.total_step_rate),
        ):
            if value is not None:
                raise InputError(
                    "the AVR firmware announces its own rates and ring (MAX_STEP_RATE, "
                    "PROFILE_STEP_RATE, TOTAL_STEP_RATE: firmware/src/config.h; BLOCK_CHUNKS: "
                    "src/step_blocks.h)",
                    source=given,
                )
        from cdprhost.sim.avr_device import run as run_avr

        return run_avr(args, faults)
    observer = None
    if args.truth:
        # imported here: its calibration statistics (scipy) cost every other start 0.7 s
        from cdprhost.sim.virtual_mocap import make_observer

        observer = make_observer(args.truth, args.mocap_dir)

    def notice(text: str) -> None:
        print(f"cdprhost sim-device: {text}", file=sys.stderr, flush=True)

    if args.ring_entries is not None and not valid_entries(args.ring_entries):
        raise InputError(
            f"{args.ring_entries} entries: a ring's size is a power of two (2..128), its "
            "counters modulo 256",
            source="--ring-entries",
        )
    rate = args.max_step_rate or SimConfig.max_step_rate
    if args.total_step_rate is not None and args.total_step_rate < rate:
        raise InputError(
            f"{args.total_step_rate} steps/s in all is under the {rate} steps/s one axis "
            "takes alone (--max-step-rate)",
            source="--total-step-rate",
        )
    try:
        device = SimDevice(
            SimConfig(
                speedup=args.speedup,
                max_step_rate=args.max_step_rate or SimConfig.max_step_rate,
                profile_step_rate=args.profile_step_rate,
                ring_entries=args.ring_entries,
                total_step_rate=args.total_step_rate,
            ),
            faults,
            observer,
            record_path=args.record,
            on_notice=notice,
        )
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", source=args.record) from None
    server = PtyServer(device, faults)

    def stop(signum: int, frame: object) -> None:
        server.stop()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    # SIGUSR1: an external reset (the DTR auto-reset a pty cannot carry), as the harness's
    signal.signal(signal.SIGUSR1, lambda signum, frame: server.request_reset())
    print(server.path, flush=True)
    print(
        f"cdprhost sim-device: {device.config.firmware_name} {device.config.firmware_version} on {server.path} "
        f"(speedup {args.speedup:g}, faults: {args.faults or 'none'})",
        file=sys.stderr,
        flush=True,
    )
    try:
        server.serve_forever()
    finally:
        server.close()
        device.close()
    return 0
