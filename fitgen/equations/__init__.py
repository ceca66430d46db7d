"""The fitted model as a typed object: its terms, its Python evaluation (double, float, fixed point), the arithmetic shared with the C, rounding bounds."""
