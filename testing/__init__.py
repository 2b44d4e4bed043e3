"""What tests and benches share: baselines to compare against (OpenCV, SCIP), camera error
measures, the photo sets fetched for the benches. Not part of the installed package."""
