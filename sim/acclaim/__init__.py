"""Acclaim (ASF skeleton + AMC motion) files: reading (``asf``, ``amc``; the values they give in
``records``) and, for the codec, writing (``writer``)."""
