"""Feed scheduling solvers: machine model, windowed LP, time reconstruction, pipeline."""
