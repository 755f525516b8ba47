"""Benchmarks: `python -m bench NAME` (or `./dev bench NAME`) prints a table and writes bench/results/NAME.json.

Each benchmark is the module bench/<name>.py (dashes in NAME become underscores) with `main(argv) -> int`.
Shared helpers (tables, JSON results, peak memory, machine facts) live in bench/common.py.
"""
