"""Non-GUI core: data model, orientation maths, filters and the processing pipeline (no Qt)."""
