"""The model to C and back: code generation, calibration blobs, identifiers, and the tooling that compiles, costs and verifies the generated C."""
