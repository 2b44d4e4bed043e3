"""Stereo line structure and motion (thesis chapter 9): the motion of a calibrated stereo rig from
lines seen in two stereo frames. Four solvers (one module each: linear, polynomial, incremental,
align), RANSAC around them (ransac), an optional refinement (refine), segment matching
(matching), and the pipeline of a frame pair (pipeline). Estimates, never certified."""
