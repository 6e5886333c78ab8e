"""Trust in the answer: Cramer-Rao standard errors, identifiability, Monte Carlo over noise realizations."""
