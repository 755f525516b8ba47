"""Benchmark `kernels`: where a skeleton stage's CPU time goes, numba kernel by numba kernel (Linux perf).

numba's machine code carries no symbols perf can read, and a kernel loaded from numba's cache keeps no object
code to name it by. This benchmark keeps the object code numba hands to LLVM as it compiles or loads each
kernel (hooked before the first one), runs the stage once so that every kernel it uses is loaded, writes
/tmp/perf-<pid>.map naming every function of every kernel's object at its loaded address (the callees compiled
into a kernel are functions of its object: they get their own rows; so do numba's reference counts,
NRT_incref and NRT_decref), records the stage again with `perf record -p` on this process (all threads), and
prints the CPU seconds sampled in each function, largest first. The rest of the samples (Python, numpy, thread
waits) is one row. Needs `perf` (Debian: linux-perf) and permission to record this
process (kernel.perf_event_paranoid <= 2 for a process of one's own).

    python -m bench kernels [--scene office-312] [--stage build|enumeration|validation] [--top 25] [--repeat 1]

Stages: `build` is build_skeleton; `enumeration` consumes core.skeleton.enumeration.iter_candidates;
`validation` validates every candidate of the scene on one thread (the candidates enumerated beforehand).
Results: bench/results/kernels-<scene>-<stage>.json.
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

from .common import Stopwatch, print_table, write_results

STAGES = ("build", "enumeration", "validation")
FREQUENCY = 999
"""Samples per second and thread: perf's default (4000) writes four times the data for no better shares."""

OUTSIDE = "(outside the kernels: Python, numpy, threads)"

_objects: dict[str, bytes] = {}


def keep_object_code() -> None:
    """Make numba hand every kernel's object code to `_objects` (library name -> ELF bytes) as it compiles or
    loads it. numba registers its hooks with LLVM when it compiles or loads its first kernel: call this before
    that."""
    from numba.core import codegen

    library_class = codegen.JITCodeLibrary
    compiled_hook = library_class._object_compiled_hook.__func__
    getbuffer_hook = library_class._object_getbuffer_hook.__func__

    def keep(ll_module, buffer):
        library = getattr(ll_module, "_CPUCodeLibrary__library", None)
        if buffer is not None and library is not None:
            _objects[library.name] = bytes(buffer)

    def compiled_and_keep(cls, ll_module, buffer):
        keep(ll_module, buffer)
        return compiled_hook(cls, ll_module, buffer)

    def getbuffer_and_keep(cls, ll_module):
        buffer = getbuffer_hook(cls, ll_module)
        keep(ll_module, buffer)
        return buffer

    library_class._object_compiled_hook = classmethod(compiled_and_keep)
    library_class._object_getbuffer_hook = classmethod(getbuffer_and_keep)


def kernel_functions() -> list[tuple[int, int, str]]:
    """(address, size, symbol) of every function in the object code of every kernel of the loaded `core`
    modules, sorted by address. Each object is placed by its kernel's own loaded address."""
    from numba.core.registry import CPUDispatcher
    from numba.core.runtime.nrt import rtsys

    placed: dict[int, tuple[int, str]] = {}

    def place(library, symbol):
        code = _objects.get(library.name)
        if code is None:
            return
        address = library.get_pointer_to_function(symbol)
        table = _object_symbols(code)
        own = [offset for offset, _, name_ in table if name_ == symbol]
        if not address or not own:
            return
        base = address - own[0]
        for offset, size, name_ in table:
            placed[base + offset] = (size, name_)

    for name, module in list(sys.modules.items()):
        if name != "core" and not name.startswith("core."):
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher):
                for compiled in value.overloads.values():
                    place(compiled.library, compiled.fndesc.llvm_func_name)
    # numba's runtime: the reference counts (atomic increments and decrements) of arrays passed between kernels
    runtime = rtsys.library
    place(runtime, "NRT_incref")
    return sorted((address, size, name_) for address, (size, name_) in placed.items())


def _object_symbols(code: bytes) -> list[tuple[int, int, str]]:
    """(offset, size, symbol) of the functions defined in an ELF object (nm)."""
    with tempfile.NamedTemporaryFile(suffix=".o") as handle:
        handle.write(code)
        handle.flush()
        listing = subprocess.run(
            ["nm", "--numeric-sort", "--print-size", "--defined-only", handle.name],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
    table = []
    for line in listing.splitlines():
        fields = line.split()
        if len(fields) == 4 and fields[2] in "tTwW":
            table.append((int(fields[0], 16), int(fields[1], 16), fields[3]))
    return table


def write_perf_map(functions: list[tuple[int, int, str]], pid: int | None = None) -> str:
    """Write /tmp/perf-<pid>.map (perf's format for code without symbols) and return its path."""
    path = f"/tmp/perf-{os.getpid() if pid is None else pid}.map"
    with open(path, "w") as out:
        for address, size, symbol in functions:
            out.write(f"{address:x} {max(size, 1):x} {symbol}\n")
    return path


def readable(symbol: str) -> str:
    """core.skeleton.validation._relaxed_arc for numba's _ZN4core8skeleton10validation12_relaxed_arcB...;
    the entry wrappers (_ZN7cpython...) get a trailing ' (wrapper)'; other symbols are returned as they are."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts = []
    at = 3
    while at < len(symbol) and symbol[at].isdigit():
        end = at
        while end < len(symbol) and symbol[end].isdigit():
            end += 1
        length = int(symbol[at:end])
        parts.append(symbol[end : end + length])
        at = end + length
    if not parts:
        return symbol
    if parts[0] == "cpython":
        return ".".join(parts[1:]) + " (wrapper)"
    return ".".join(parts)


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench kernels", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="office-312", help="a scene of bench/scenes.py (default office-312)")
    parser.add_argument("--stage", choices=STAGES, default="build")
    parser.add_argument("--top", type=int, default=25, help="functions listed (the rest summed in one row)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs of the stage recorded (a small scene's one run gives too few samples)")
    args = parser.parse_args(argv)
    if shutil.which("perf") is None or shutil.which("nm") is None:
        print("bench kernels needs Linux perf and nm on PATH (Debian: linux-perf, binutils)", file=sys.stderr)
        return 2
    keep_object_code()

    from .scenes import SCENES

    if args.scene not in SCENES:
        print(f"unknown scene {args.scene!r}; scenes: {', '.join(sorted(SCENES))}", file=sys.stderr)
        return 2
    run = _stage(args.stage, SCENES[args.scene]().build())
    with Stopwatch() as warm_up:
        run()
    functions = kernel_functions()
    if not functions:
        print("no kernel object code was kept: numba loaded kernels before keep_object_code()", file=sys.stderr)
        return 1
    map_path = write_perf_map(functions)
    with tempfile.TemporaryDirectory() as folder:
        data = os.path.join(folder, "perf.data")
        recorder = subprocess.Popen(
            ["perf", "record", "--freq", str(FREQUENCY), "--pid", str(os.getpid()), "--output", data, "--quiet"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        # perf attaches to the running threads after it starts: give it a moment
        time.sleep(1.0)
        with Stopwatch() as timed:
            for _ in range(args.repeat):
                run()
        recorder.send_signal(signal.SIGINT)
        _, errors = recorder.communicate()
        if recorder.returncode not in (0, -signal.SIGINT) or not os.path.exists(data):
            print(f"perf record failed: {errors.decode(errors='replace').strip()}", file=sys.stderr)
            return 1
        report = subprocess.run(
            ["perf", "report", "--input", data, "--stdio", "--no-children", "--sort", "symbol",
             "--field-separator", "\t", "--show-nr-samples"],
            capture_output=True, text=True,
        )  # fmt: skip
    os.unlink(map_path)
    if report.returncode != 0:
        print(f"perf report failed: {report.stderr.strip()}", file=sys.stderr)
        return 1
    samples = _samples_by_function(report.stdout, {symbol for _, _, symbol in functions})
    rows = _rows(samples, args.top)
    print_table(rows, ["function", "cpu_seconds", "share"],
                title=f"CPU time by numba function: {args.repeat} x {args.stage} of {args.scene} "
                      f"({timed.seconds:.2f} s wall, sampled at {FREQUENCY} Hz per thread)")  # fmt: skip
    write_results(f"kernels-{args.scene}-{args.stage}", rows, scene=args.scene, stage=args.stage,
                  repeat=args.repeat, wall_seconds=timed.seconds, warm_up_seconds=warm_up.seconds,
                  frequency=FREQUENCY)  # fmt: skip
    return 0


def _stage(stage: str, scene):
    from core.skeleton import build_skeleton

    if stage == "build":
        return lambda: build_skeleton(scene)
    from core.skeleton.enumeration import iter_candidates

    empty = build_skeleton(scene, sources=[])
    if stage == "enumeration":
        return lambda: sum(len(chunk) for chunk, _ in iter_candidates(scene, empty.vertex_mask, empty.edge_mask))
    from core.skeleton.candidates import NodeCandidates
    from core.skeleton.validation import element_solids, validate_candidates

    chunks = [chunk for chunk, _ in iter_candidates(scene, empty.vertex_mask, empty.edge_mask)]
    candidates = NodeCandidates.concatenate(chunks)
    solid = element_solids(scene, empty.topology)
    return lambda: validate_candidates(scene, empty.topology, empty.bvh, candidates, empty.edge_mask, workers=1,
                                       element_solid=solid)  # fmt: skip


def _samples_by_function(report: str, known: set[str]) -> dict[str, int]:
    """Samples per readable function name from `perf report --field-separator '\\t' --show-nr-samples`; the
    symbols not in `known` (those of the perf map) are summed as OUTSIDE."""
    samples: dict[str, int] = {}
    for line in report.splitlines():
        if not line or line.startswith("#"):
            continue
        fields = line.split("\t")
        if len(fields) < 3:
            continue
        count = int(fields[1])
        symbol = fields[2].split("] ", 1)[-1].strip()
        name = readable(symbol) if symbol in known else OUTSIDE
        samples[name] = samples.get(name, 0) + count
    return samples


def _rows(samples: dict[str, int], top: int) -> list[dict]:
    total = sum(samples.values())
    outside = samples.pop(OUTSIDE, 0)
    ranked = sorted(samples.items(), key=lambda item: -item[1])
    listed = ranked[:top]
    rest = sum(count for _, count in ranked[top:])
    rows = [{"function": name, "samples": count} for name, count in listed]
    if rest:
        rows.append({"function": f"({len(ranked) - top} other functions)", "samples": rest})
    rows.append({"function": OUTSIDE, "samples": outside})
    for row in rows:
        row["cpu_seconds"] = row["samples"] / FREQUENCY
        row["share"] = f"{100.0 * row['samples'] / max(total, 1):.1f} %"
    return rows
