"""What it would cost to log the messages Zenoh drops for being over the size limit.

Run: ``python -m plumeswarm.bench.rxtrace [-n 20000] [--size 300] [--rounds 3] [--out DIR]``.
Zenoh (eclipse-zenoh 1.10) names a message over ``[network] max_message_size_bytes`` only in a
TRACE event of the target :data:`TARGET` (``Defragmentation buffer full: N bytes. Capacity:
C.``); that target also traces every batch a session receives, with its bytes. Each row is a
fresh process: one session puts ``-n`` payloads of ``--size`` bytes to another over TCP on
loopback, with that target off, or traced to the process's standard output read through a pipe
and scanned for the drop (as ``swarmbus.refusals`` reads the access-control trace). Prints the
seconds until the last payload arrived and the bytes of trace; writes ``rxtrace.json`` in
``--out``. No assertions.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

from swarmbus.session import NetworkConfig, free_tcp_port, open_session

TARGET = "zenoh_transport::unicast::universal::rx"
DROP = b"Defragmentation buffer full"


def _scan(fd: int, counts: dict[str, int]) -> None:
    """Read the trace from ``fd`` until it closes: its bytes, and the drops it names."""
    rest = b""
    while chunk := os.read(fd, 1 << 16):
        counts["bytes"] += len(chunk)
        lines = (rest + chunk).split(b"\n")
        rest = lines.pop()
        counts["drops"] += sum(DROP in line for line in lines)


def one_run(n: int, size: int, traced: bool) -> dict[str, float | int]:
    """In this process: ``n`` puts of ``size`` bytes, the target traced or not."""
    counts = {"bytes": 0, "drops": 0}
    reader = None
    if traced:
        sys.stdout.flush()
        saved = os.dup(1)
        read_fd, write_fd = os.pipe()
        os.dup2(write_fd, 1)
        os.close(write_fd)
        reader = threading.Thread(target=_scan, args=(read_fd, counts), daemon=True)
        reader.start()
        zenoh.init_log_from_env_or(f"{TARGET}=trace")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    got = threading.Event()
    received = [0]

    def on_sample(_: zenoh.Sample) -> None:
        received[0] += 1
        if received[0] == n:
            got.set()

    with (
        open_session(NetworkConfig(mode="peer", listen=[endpoint], connect=[])) as sink,
        open_session(NetworkConfig(mode="peer", listen=[], connect=[endpoint])) as source,
    ):
        sub = sink.declare_subscriber("bench/rxtrace", on_sample)
        pub = source.declare_publisher(
            "bench/rxtrace", congestion_control=zenoh.CongestionControl.BLOCK
        )
        deadline = time.monotonic() + 30.0
        while not getattr(pub.matching_status, "matching", False):
            if time.monotonic() > deadline:
                raise RuntimeError("the two sessions did not match")
            time.sleep(0.05)
        payload = bytes(size)
        t0 = time.perf_counter()
        for _ in range(n):
            pub.put(payload)
        if not got.wait(120.0):
            raise RuntimeError(f"{received[0]} of {n} payloads arrived")
        seconds = time.perf_counter() - t0
        sub.undeclare()
    if reader is not None:
        sys.stdout.flush()
        os.dup2(saved, 1)  # the pipe's last writer: the reader ends
        reader.join(10.0)
    return {"seconds": seconds, "trace_bytes": counts["bytes"], "drops_named": counts["drops"]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("-n", type=int, default=20_000, help="payloads per run")
    p.add_argument("--size", type=int, default=300, help="bytes per payload")
    p.add_argument("--rounds", type=int, default=3, help="runs of each row, interleaved")
    p.add_argument("--out", type=Path, default=None, help="directory of rxtrace.json")
    p.add_argument("--one", choices=["off", "traced"], help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one:  # a row's run, in a process of its own (Zenoh's log cannot be turned off)
        row = one_run(args.n, args.size, args.one == "traced")
        print(json.dumps(row), file=sys.stderr)
        return
    rows: dict[str, list[dict[str, float | int]]] = {"off": [], "traced": []}
    for _ in range(args.rounds):  # interleaved: a shared machine's load drifts
        for name, runs in rows.items():
            cmd = [sys.executable, "-m", __spec__.name if __spec__ else "plumeswarm.bench.rxtrace"]
            cmd += ["-n", str(args.n), "--size", str(args.size), "--one", name]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=True)
            runs.append(json.loads(res.stderr.strip().splitlines()[-1]))
    print(f"{args.n} puts of {args.size} B, TCP on loopback, {args.rounds} runs per row")
    print(f"{TARGET + ' trace':52} {'seconds':>15} {'trace MB':>9}")
    for name, runs in rows.items():
        secs = sorted(float(r["seconds"]) for r in runs)
        mb = max(int(r["trace_bytes"]) for r in runs) / 1e6
        print(f"{name:52} {secs[0]:6.3f}–{secs[-1]:6.3f}   {mb:9.1f}")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        summary = {"n": args.n, "size": args.size, "target": TARGET, "runs": rows}
        (args.out / "rxtrace.json").write_text(json.dumps(summary, indent=2))
        print(f"wrote {args.out / 'rxtrace.json'}")


if __name__ == "__main__":
    main()
