"""One calibration path for every source of points (bags, simulations, tables)."""
