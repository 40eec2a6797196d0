"""Workflows that chain the stages: read -> estimate -> monitor -> diagnose -> store -> report.

Stages never call a later one; the flows that do (a check stored in the
history, the demo, a fleet run) live here.
"""
