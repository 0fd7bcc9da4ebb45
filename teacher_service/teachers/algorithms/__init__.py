"""The teachers' algorithms apart from their adapters: CURROT's particle update and ALP-GMM's
learning-progress history. The adapters in ``teachers`` hold the parameters, count results, let
fits fall due, install them and save and restore their state."""
