"""The ground floor: one-line input errors, atomic file writes, terminal progress, option parsing shared by every layer."""
