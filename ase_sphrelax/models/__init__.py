"""Method models: the physics of each method, shared by its calculator, drivers and tools."""
