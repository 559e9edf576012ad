"""Engine tier."""
