"""Benchmarks and developer tools for lfcodec."""
