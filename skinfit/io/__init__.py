"""The files a researcher edits (model cards, prior files, datasets, the campaign file)
read into frozen, validated objects in SI units; search paths, units, the role registry."""
