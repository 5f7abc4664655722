"""Shipped SUMO networks: one folder per network (plain XML sources, built .net.xml, polygons, scenario.toml)."""
