// Build-time stand-in for three's STLLoader and ColladaLoader, which urdf-loader imports for its
// default mesh loader. viewer3d.js never fetches meshes (it sets loadMeshCb), so these keep the
// bundle small. Aliased in by build.sh.
class NoMeshLoader {
    constructor() {}
    load(url, onLoad, onProgress, onError) {
        if (onError) onError(new Error('EezyViewer3D: mesh loading is not bundled: ' + url));
    }
}
export { NoMeshLoader as STLLoader, NoMeshLoader as ColladaLoader };
