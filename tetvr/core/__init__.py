"""The small value objects every stage uses, and nothing else: the camera, the image helpers,
clip regions, opaque surfaces, eye rays, and the argument checks. Imports no other part of tetvr."""
