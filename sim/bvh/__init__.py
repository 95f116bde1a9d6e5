"""BVH motion capture files: read (:mod:`sim.bvh.reader`), turned into the Acclaim records every
downstream step takes (:mod:`sim.bvh.convert`), and written (:mod:`sim.bvh.writer`)."""
