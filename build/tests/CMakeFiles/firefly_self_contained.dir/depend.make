# Empty dependencies file for firefly_self_contained.
# This may be replaced when dependencies are built.
