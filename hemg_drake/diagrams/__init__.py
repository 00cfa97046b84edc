"""Diagram builders: one function per diagram."""
