"""CLI command modules; each exposes ``register(subparsers)`` (see stimuli.cli)."""
