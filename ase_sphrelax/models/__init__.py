"""Array-level physics of the methods (any dimension), used by their calculators and drivers."""
