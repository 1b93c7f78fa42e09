"""Looks, YAML presets and batches: what runs effects on frames."""
