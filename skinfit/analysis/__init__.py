"""Fits in, results out: evidence, comparison, the misfit check, SBC, groups of
fits, contrasts, populations and experimental design."""
