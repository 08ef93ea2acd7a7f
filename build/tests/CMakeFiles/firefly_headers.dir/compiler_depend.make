# Empty custom commands generated dependencies file for firefly_headers.
# This may be replaced when dependencies are built.
