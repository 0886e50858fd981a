//! `ptm-bake`: Embree 4 occlusion baking of tileable swatches from a dome of lights.
