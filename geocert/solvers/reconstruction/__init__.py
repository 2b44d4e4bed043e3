"""From correspondences or photos to a certified metric reconstruction (issue 14)."""
