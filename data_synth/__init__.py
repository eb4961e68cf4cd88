"""Build and check the synthetic regression puzzles (smoke set for tests, bench set for benchmarks)."""
