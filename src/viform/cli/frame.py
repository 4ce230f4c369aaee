"""CLI commands: frame (registered on viform.cli.app.cli)."""
