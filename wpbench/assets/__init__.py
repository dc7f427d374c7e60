"""Furniture and object assets: procedural furniture, Ravens objects, real PartNet-Mobility folders."""
