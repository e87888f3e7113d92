// Independent VRML 2.0 check: parses a .wrl with Coin3D (Open Inventor with VRML97 support,
// Debian package libcoin-dev), then traverses the scene with a callback action and prints, as
// JSON, how many triangles Coin generates and how many VRML IndexedFaceSets and ImageTextures
// it found. Exit 1 if Coin cannot read the file.
// Build: g++ -O1 -o vrml_check vrml_check.cpp -lCoin
#include <Inventor/SoDB.h>
#include <Inventor/SoInput.h>
#include <Inventor/SoPrimitiveVertex.h>
#include <Inventor/actions/SoCallbackAction.h>
#include <Inventor/nodes/SoSeparator.h>
#include <Inventor/VRMLnodes/SoVRMLIndexedFaceSet.h>
#include <Inventor/VRMLnodes/SoVRMLImageTexture.h>
#include <cstdio>

static long triangles = 0;
static long face_sets = 0;
static long textures = 0;

static void on_triangle(void*, SoCallbackAction*, const SoPrimitiveVertex*, const SoPrimitiveVertex*,
                        const SoPrimitiveVertex*) {
  triangles++;
}
static SoCallbackAction::Response on_face_set(void*, SoCallbackAction*, const SoNode*) {
  face_sets++;
  return SoCallbackAction::CONTINUE;
}
static SoCallbackAction::Response on_texture(void*, SoCallbackAction*, const SoNode*) {
  textures++;
  return SoCallbackAction::CONTINUE;
}

int main(int argc, char** argv) {
  if (argc != 2) { std::fprintf(stderr, "usage: vrml_check FILE.wrl\n"); return 2; }
  SoDB::init();
  SoInput in;
  if (!in.openFile(argv[1])) { std::fprintf(stderr, "cannot open %s\n", argv[1]); return 1; }
  if (!in.isFileVRML2()) { std::fprintf(stderr, "%s is not VRML 2.0\n", argv[1]); return 1; }
  SoSeparator* root = SoDB::readAll(&in);
  if (!root) { std::fprintf(stderr, "Coin could not parse %s\n", argv[1]); return 1; }
  root->ref();
  SoCallbackAction ca;
  ca.addTriangleCallback(SoVRMLIndexedFaceSet::getClassTypeId(), on_triangle, NULL);
  ca.addPreCallback(SoVRMLIndexedFaceSet::getClassTypeId(), on_face_set, NULL);
  ca.addPreCallback(SoVRMLImageTexture::getClassTypeId(), on_texture, NULL);
  ca.apply(root);
  std::printf("{\"triangles\": %ld, \"face_sets\": %ld, \"textures\": %ld}\n", triangles, face_sets, textures);
  root->unref();
  return 0;
}
