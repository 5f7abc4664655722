"""Bridges to other tracking frameworks (each behind its own optional extra)."""
