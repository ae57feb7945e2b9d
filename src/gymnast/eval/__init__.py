"""Evaluation on the real world: success rates with confidence intervals, videos, reports."""
