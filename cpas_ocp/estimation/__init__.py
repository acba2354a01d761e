"""The estimator: the offline reduction and initial guess, the shooting grid, the multiple-
shooting NLP and its functions, the solve with its stopping rule and the feasible
descent that finishes it, the linearisation and the covariance, and the forward
simulation.
"""
