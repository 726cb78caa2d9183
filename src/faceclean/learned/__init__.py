"""The learned cleaners' runtime (numpy, numba, ONNX); never torch."""
