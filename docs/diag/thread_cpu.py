"""Run a command; poll /proc every 0.2 s; print the CPU seconds of each of its threads and
of its child processes' threads (docs/live_measurements.md, "Offline and live check on the
tenth-session tree": where a replay's CPU goes). Linux only.

Usage: python docs/diag/thread_cpu.py COMMAND [ARG...]
e.g.   python docs/diag/thread_cpu.py .venv/bin/mbtrack replay /tmp/ilive/live1800 --out O
           --seed 0 --params config/clear_room_offline.yaml
Prints the command's last line of stderr, then "pid tid name cpu_seconds" per thread that
used at least 0.05 s (the main thread's tid equals its pid).
"""
import os
import subprocess
import sys
import time

TICK = os.sysconf('SC_CLK_TCK')


def scan(pid: int, seen: dict) -> None:
    """CPU so far of every thread of ``pid`` and of its children, into ``seen``."""
    try:
        for tid in os.listdir(f'/proc/{pid}/task'):
            try:
                stat = open(f'/proc/{pid}/task/{tid}/stat').read()
            except OSError:
                continue
            name = stat[stat.index('(') + 1:stat.rindex(')')]
            fields = stat[stat.rindex(')') + 2:].split()
            seen[(pid, int(tid))] = (name, (int(fields[11]) + int(fields[12])) / TICK)
        for child in open(f'/proc/{pid}/task/{pid}/children').read().split():
            scan(int(child), seen)
    except OSError:
        pass


def main() -> int:
    proc = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    seen: dict = {}
    while proc.poll() is None:
        scan(proc.pid, seen)
        time.sleep(0.2)
    err = proc.stderr.read().decode().strip()
    print(err.splitlines()[-1] if err else '')
    for (pid, tid), (name, cpu) in sorted(seen.items()):
        if cpu >= 0.05:
            print(pid, tid, name, f'{cpu:.2f}')
    return proc.returncode


if __name__ == '__main__':
    sys.exit(main())
