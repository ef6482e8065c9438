"""Pigment libraries: constants per pigment from all its films, prediction and matching of recipes."""
