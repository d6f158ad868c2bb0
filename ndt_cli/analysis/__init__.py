"""The paper's experiments on the user's scans, and accuracy against reference poses."""
