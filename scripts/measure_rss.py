"""Resident memory of a command and its child processes over time (the memory figures of README "What survives
what"): ``python scripts/measure_rss.py gyro-sim run spinup_thin_shell --duration 3600 --record bag --quiet``.

Samples the summed RSS every 2 wall seconds (psutil) and prints the command's last output, its exit status, a
dozen of the samples and min / max after the first fifth of the run (start-up left out)."""
import subprocess
import sys
import time

import psutil


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ps = psutil.Process(proc.pid)
    rows = []
    t0 = time.monotonic()
    while proc.poll() is None:
        try:
            rss = ps.memory_info().rss + sum(c.memory_info().rss for c in ps.children(recursive=True))
        except psutil.Error:
            break
        rows.append((time.monotonic() - t0, rss / 2**20))
        time.sleep(2)
    print(proc.stdout.read()[-1500:])
    print("exit status", proc.wait())
    for t, m in rows[:: max(1, len(rows) // 12)]:
        print(f"{t:7.1f} s  {m:8.1f} MiB")
    after = rows[len(rows) // 5:]
    if after:
        print(f"after start-up: min {min(m for _, m in after):.1f} MiB, max {max(m for _, m in after):.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
