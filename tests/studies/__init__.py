"""Scenario and recovery studies: each fits whole phases, diagnoses or discovers, against a
synthetic truth or a real flight; all marked slow (left out of the fast tier)."""
