"""Certified bilinear fitting (thesis chapter 8, appendix C): a shape as a combination of K basis
shapes, seen by an affine camera; camera and coefficients to a certified global optimum by branch
and bound on the camera alone (search), on the problem and relaxation of
geocert.formulations.bilinear."""
