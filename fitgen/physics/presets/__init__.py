"""Bundled sensor description files (TOML)."""
