"""Losses of the fusion method, each a function of tensors (docs/method.md sections 1-4).

- :mod:`fusiongs.losses.blur`: exposure-integrated blur model and blur loss.
- :mod:`fusiongs.losses.event`: rendered log change, mse / band / pvc event losses, pixel sampling.
- :mod:`fusiongs.losses.colour`: CFA layouts, bilinear demosaic of event maps, channel weights.
- :mod:`fusiongs.losses.threshold`: the learnable contrast threshold module.
- :mod:`fusiongs.losses.priors`: EDI and HPF-intensity priors.
"""
