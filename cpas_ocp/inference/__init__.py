"""What a fit supports: whether it is a result, continuation and restarts, phase windows
and residual statistics, likelihood-ratio laws, model comparison, profile likelihoods,
what-if constraints, and the wind process's intensity.
"""
