"""The benchmark: procedural test shapes (:mod:`.shapes`), a virtual scanner (:mod:`.scan`), the
seeded data sets and scan conditions (:mod:`.dataset`) and the scoring harness (:mod:`.harness`).

Never imported when reconstructing; never imports bpy.
"""
