# Empty dependencies file for firefly_tests.
# This may be replaced when dependencies are built.
