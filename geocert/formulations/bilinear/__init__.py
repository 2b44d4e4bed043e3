"""Bilinear fitting (thesis chapter 8, appendix C), the part the solver and the verifier share: the
problem and its frames (problem), the relaxation of a box of cameras (relaxation), the options and
the determinacy estimates."""
