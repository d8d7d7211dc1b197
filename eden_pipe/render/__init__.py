"""Renderers and their lighting (sky, sun, scenery)."""
