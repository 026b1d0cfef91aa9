"""Training of the shipped labeler models (PyTorch, CPU). Never imported by the add-on's core.

``python -m training --all`` (``make models``) rebuilds every shipped model; see :mod:`.recipes`.
"""
