"""CLI commands: gated (registered on viform.cli.app.cli)."""
