"""The `cdam` command line: one module per command in this package.

Each command module defines ``register(subparsers)``, which adds its sub-parser and sets
``func`` (called with the parsed namespace, returning an exit code).
"""
