"""Measurements apart from the pipeline: benchmarks, experiments (the paper's tables and
plots), accuracy trades. The pipeline never imports this package.
"""
