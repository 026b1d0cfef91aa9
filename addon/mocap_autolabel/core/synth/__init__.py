"""Synthetic takes made by the project itself (no third-party data)."""
