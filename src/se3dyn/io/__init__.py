"""Files: model files (``modelfile``: YAML/JSON, schema, reference) and results files (``h5``:
HDF5 written while a run goes, resumable). Importers (URDF) will live here."""
