"""What one large message costs a receiving process in resident memory.

Run: ``python -m plumeswarm.bench.rxmemory [--mib 16 64 120 127 129] [--out DIR]``. Each row
is a fresh receiving process (a peer with the default ``[network]`` limits: 32 MiB refused with
a line, 128 MiB Zenoh's transport limit) whose subscriber passes every sample through
``swarmbus.session.payload_or_none`` and keeps what it accepts; a sending peer whose own limit
is 1 GiB puts two payloads of ``--mib`` MiB (congestion control ``block``), then a marker. The
receiver's resident memory is sampled every 10 ms. Prints its growth and what the subscriber
got; writes ``rxmemory.json`` in ``--out``. No assertions.
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import zenoh

from swarmbus.session import NetworkConfig, free_tcp_port, open_session, payload_or_none

MIB = 2**20
KEY = "bench/rxmemory"
MARKER = b"end"


def receive(endpoint: str) -> None:
    """The receiving process: listen on ``endpoint``, say ``ready``, print the sizes got."""
    log = logging.getLogger("bench.rxmemory")
    got: list[int | None] = []
    done = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "a payload", log)
        got.append(None if data is None else len(data))
        if data == MARKER:
            done.set()

    with open_session(NetworkConfig(mode="peer", listen=[endpoint], shared_memory=False)) as s:
        sub = s.declare_subscriber(KEY, on_sample)
        print("ready", flush=True)
        done.wait(120.0)
        sub.undeclare()
    print(json.dumps(got), flush=True)


def one_row(mib: int) -> dict[str, object]:
    """Two puts of ``mib`` MiB and a marker to a fresh receiving process."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    cmd = [sys.executable, "-m", "plumeswarm.bench.rxmemory", "--receive", endpoint]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        if proc.stdout.readline().strip() != "ready":
            raise RuntimeError("the receiving process did not start")
        watched = psutil.Process(proc.pid)
        start = peak = watched.memory_info().rss
        stop = threading.Event()

        def sample_rss() -> None:
            nonlocal peak
            while not stop.wait(0.01):
                try:
                    peak = max(peak, watched.memory_info().rss)
                except psutil.Error:
                    return

        sampler = threading.Thread(target=sample_rss, daemon=True)
        sampler.start()
        rogue = NetworkConfig(
            mode="peer", connect=[endpoint], max_message_size_bytes=2**30, shared_memory=False
        )
        with open_session(rogue) as sender:
            pub = sender.declare_publisher(KEY, congestion_control=zenoh.CongestionControl.BLOCK)
            deadline = time.monotonic() + 30.0
            while not getattr(pub.matching_status, "matching", False):
                if time.monotonic() > deadline:
                    raise RuntimeError("the two sessions did not match")
                time.sleep(0.05)
            for _ in range(2):
                pub.put(bytes(mib * MIB))
            pub.put(MARKER)
            out, _ = proc.communicate(timeout=120)
        stop.set()
        sampler.join(5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    got = json.loads(out.strip().splitlines()[-1])
    return {"mib": mib, "start_bytes": start, "peak_bytes": peak, "got": got}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--mib", type=int, nargs="+", default=[16, 64, 120, 127, 129])
    p.add_argument("--out", type=Path, default=None, help="directory of rxmemory.json")
    p.add_argument("--receive", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.receive:
        receive(args.receive)
        return
    rows = [one_row(mib) for mib in args.mib]
    print("two payloads then a marker to a fresh peer (default limits), TCP on loopback")
    print(f"{'payload MiB':>11} {'start MB':>9} {'peak MB':>8} {'growth MiB':>11}  got")
    for r in rows:
        start, peak = int(r["start_bytes"]), int(r["peak_bytes"])  # type: ignore[call-overload]
        growth = (peak - start) / MIB
        print(f"{r['mib']:>11} {start / 1e6:9.1f} {peak / 1e6:8.1f} {growth:11.1f}  {r['got']}")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "rxmemory.json").write_text(json.dumps(rows, indent=2))
        print(f"wrote {args.out / 'rxmemory.json'}")


if __name__ == "__main__":
    main()
