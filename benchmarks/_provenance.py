"""Provenance recorded in every benchmark's JSON."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path


def git_version():
    """``git describe --always --dirty`` of the checkout (uncommitted core changes show as -dirty)."""
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], cwd=Path(__file__).resolve().parent,
                              capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _cpuinfo():
    """The first processor's fields of ``/proc/cpuinfo`` (empty where there is none)."""
    fields = {}
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return fields
    for line in text.split("\n\n")[0].splitlines():
        key, _, value = line.partition(":")
        fields[key.strip()] = value.strip()
    return fields


def _cache_kib(level):
    """Size in KiB of cpu0's unified (or data) cache of ``level`` from sysfs; None where not known."""
    root = Path("/sys/devices/system/cpu/cpu0/cache")
    for index in sorted(root.glob("index*")):
        try:
            if int((index / "level").read_text()) == level and (index / "type").read_text().strip() != "Instruction":
                size = (index / "size").read_text().strip()
                return int(size[:-1]) * (1024 if size.endswith("M") else 1) if size[-1] in "KM" else int(size) // 1024
        except (OSError, ValueError):
            continue
    return None


def machine():
    """What a timing depends on besides the code: the CPU (model, the target numba compiles for and its widest
    vector instructions), its caches, the logical CPUs and the load average now.

    Two timings are comparable only when ``same_machine`` holds for their records: the same code took 28 s on one
    machine of this project's kind and 54 s on another (``reproductions/speed-fan-1e6``)."""
    info = _cpuinfo()
    flags = set(info.get("flags", "").split())
    try:
        import llvmlite.binding as llvm

        target = llvm.get_host_cpu_name()
    except Exception:  # noqa: BLE001 (no llvmlite: the record says so)
        target = None
    return dict(cpu=info.get("model name"), cpu_family=info.get("cpu family"), cpu_model=info.get("model"),
                compile_target=target, vector="avx512" if "avx512f" in flags else "avx2" if "avx2" in flags
                else "other", mhz=float(info["cpu MHz"]) if "cpu MHz" in info else None,
                l2_kib=_cache_kib(2), l3_kib=_cache_kib(3), cpus=os.cpu_count(),
                load_average=list(os.getloadavg()) if hasattr(os, "getloadavg") else None)


MACHINE_KEYS = ("cpu", "cpu_family", "cpu_model", "compile_target", "vector", "l2_kib", "l3_kib", "cpus")
"""The fields of :func:`machine` that name the machine (not its clock reading or load at the time)."""


def same_machine(a, b):
    """True when the records ``a`` and ``b`` of :func:`machine` name the same kind of machine; False when either is
    missing (a timing stored without its machine is compared with nothing)."""
    return bool(a) and bool(b) and all(a.get(k) == b.get(k) for k in MACHINE_KEYS)


def write_json(path, data):
    """Write a benchmark's results (creating the folder) and say where."""
    import json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))
    print(f"wrote {path}")
