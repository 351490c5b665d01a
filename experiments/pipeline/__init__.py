"""The work behind `trunkslam extract` and `trunkslam slam`: read a sequence file, run the
extractor or the filter, write the results (one function each, so the CLI only parses)."""
