"""Automatic differentiation of kernels: IR-to-IR transforms (reverse mode) and their derivative rules.
The user-facing Tape lives in lang/tape.py (it records kernel launches through lang/ad_hooks)."""
