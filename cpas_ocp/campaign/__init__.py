"""Many tests at once: campaigns run in parallel, parameter distributions across tests,
convex hulls, Monte Carlo dispersions, drag-area envelopes, peak-load studies and
configuration ratios.
"""
