"""Stratified autocalibration (thesis chapter 6, appendix B): the plane at infinity from the
modulus constraints, then the DIAC, each to certified global optimality."""
