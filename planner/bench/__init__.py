"""Benchmarks and the batch runner, outside the library's core."""
