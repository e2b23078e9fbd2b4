"""Helpers shared by test files (no test imports another test file): each module one idea."""
