"""The physics of a test phase: the atmosphere, units, named parameters, the canopies'
inflation laws, the effects (one file each, in `effects/`) and their composition into
the dynamics and the sensor predictions.
"""
