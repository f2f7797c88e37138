"""Analysis: metrics, identification, generalization, diagnosis, cross-checks."""
