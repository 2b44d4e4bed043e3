"""From correspondences or photos to a certified metric reconstruction: the estimators the
pipeline (geocert.pipelines.reconstruction) calls, on the claims of
geocert.formulations.reconstruction."""
